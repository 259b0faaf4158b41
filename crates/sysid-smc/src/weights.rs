//! Log-domain weights: normalisation, effective sample size and categorical draws.

use crate::vexp::exp_shifted_sum;

/// The largest value of a slice (`-inf` for an empty slice or all `-inf`).
/// NaN entries are ignored; callers check for them separately.
#[inline(always)]
pub fn max_value(values: &[f64]) -> f64 {
    let mut acc = [f64::NEG_INFINITY; 4];
    let mut chunks = values.chunks_exact(4);
    for c in &mut chunks {
        for (a, &x) in acc.iter_mut().zip(c) {
            *a = if x > *a { x } else { *a };
        }
    }
    let mut m = acc[0].max(acc[1]).max(acc[2].max(acc[3]));
    for &x in chunks.remainder() {
        m = if x > m { x } else { m };
    }
    m
}

/// Normalises log-weights.
///
/// Writes the normalised weights `W_i = exp(l_i) / sum_j exp(l_j)` into `weights` and
/// returns `log sum_j exp(l_j)`, computed stably (shifted by the maximum). Returns
/// `None` when every log-weight is `-inf`.
///
/// # Example
/// ```
/// let mut w = [0.0; 2];
/// let log_sum = sysid_smc::normalise_log_weights(&[0.0, 2f64.ln()], &mut w).unwrap();
/// assert!((log_sum - 3f64.ln()).abs() < 1e-15);
/// assert!((w[1] - 2.0 / 3.0).abs() < 1e-15);
/// ```
#[inline]
pub fn normalise_log_weights(log_weights: &[f64], weights: &mut [f64]) -> Option<f64> {
    let max = max_value(log_weights);
    if max == f64::NEG_INFINITY {
        return None;
    }
    weights.copy_from_slice(log_weights);
    let sum = exp_shifted_sum(weights, max);
    let scale = 1.0 / sum;
    for w in weights.iter_mut() {
        *w *= scale;
    }
    Some(max + sum.ln())
}

/// Effective sample size `1 / sum W_i^2` of normalised weights.
#[inline]
pub fn effective_sample_size(weights: &[f64]) -> f64 {
    1.0 / sum_of_squares(weights)
}

/// `sum W_i^2`, with four interleaved partial sums (a fixed order).
#[inline(always)]
pub fn sum_of_squares(weights: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut chunks = weights.chunks_exact(4);
    for c in &mut chunks {
        for (a, &w) in acc.iter_mut().zip(c) {
            *a += w * w;
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|w| w * w).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Index `i` with `sum_{j<i} w_j <= target < sum_{j<=i} w_j`, for non-negative weights.
///
/// Scans blocks of eight (block sums are independent, so only the block totals form a
/// dependency chain). A target at or beyond the total (rounding) gives the last index
/// with positive weight.
#[inline(always)]
pub fn find_cumulative(weights: &[f64], target: f64) -> usize {
    let mut acc = 0.0;
    let mut start = 0;
    for block in weights.chunks(8) {
        let s = block_sum(block);
        if acc + s > target {
            for (k, &w) in block.iter().enumerate() {
                acc += w;
                if acc > target {
                    return start + k;
                }
            }
        } else {
            acc += s;
        }
        start += block.len();
    }
    weights.iter().rposition(|&w| w > 0.0).unwrap_or(0)
}

/// Sum of up to eight values as a balanced tree (no long dependency chain).
#[inline(always)]
fn block_sum(block: &[f64]) -> f64 {
    if let Ok(b) = <&[f64; 8]>::try_from(block) {
        ((b[0] + b[4]) + (b[1] + b[5])) + ((b[2] + b[6]) + (b[3] + b[7]))
    } else {
        block.iter().sum()
    }
}

/// The total of non-negative weights, as the sum of the same block sums that
/// [`find_cumulative`] scans, so that `uniform * total` always falls inside.
#[inline(always)]
pub fn blocked_total(weights: &[f64]) -> f64 {
    weights.chunks(8).map(block_sum).sum()
}

/// Draws an index with probabilities proportional to the non-negative `weights`, or
/// `None` when their total is not a positive finite number (NaN weights, all zero).
#[inline(always)]
pub fn draw_from_weights(weights: &[f64], uniform: f64) -> Option<usize> {
    let total = blocked_total(weights);
    (total > 0.0 && total.is_finite()).then(|| find_cumulative(weights, uniform * total))
}

/// Shifts every row of a row-major matrix of log-weights by its maximum, so that the
/// largest entry of each row is 0. Returns the index of a row whose maximum is `-inf`
/// (degenerate) or `+inf` (invalid). NaN entries survive as NaN and are caught by the
/// caller after exponentiation.
#[inline(always)]
pub fn shift_rows_by_max(matrix: &mut [f64], row_len: usize) -> Result<(), (usize, DrawFailure)> {
    for (k, row) in matrix.chunks_exact_mut(row_len).enumerate() {
        let max = checked_row_max(row).map_err(|f| (k, f))?;
        for v in row.iter_mut() {
            *v -= max;
        }
    }
    Ok(())
}

/// The maximum of a row of log-weights, or why no draw is possible from it: every
/// entry `-inf` (degenerate) or some entry `+inf` (invalid). NaN entries are ignored.
#[inline(always)]
pub fn checked_row_max(row: &[f64]) -> Result<f64, DrawFailure> {
    match max_value(row) {
        f64::NEG_INFINITY => Err(DrawFailure::Degenerate),
        f64::INFINITY => Err(DrawFailure::Invalid),
        max => Ok(max),
    }
}

/// Why a categorical draw from log-weights failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DrawFailure {
    /// Every log-weight is `-inf`.
    Degenerate,
    /// A log-weight is NaN or `+inf`.
    Invalid,
}

/// Draws an index with probabilities proportional to `exp(log_weights[i])`,
/// overwriting `log_weights` with the unnormalised weights. `uniform` is in [0, 1).
#[inline]
pub fn draw_from_log_weights(log_weights: &mut [f64], uniform: f64) -> Result<usize, DrawFailure> {
    let max = max_value(log_weights);
    if max == f64::NEG_INFINITY {
        return Err(DrawFailure::Degenerate);
    }
    if max == f64::INFINITY {
        return Err(DrawFailure::Invalid);
    }
    exp_shifted_sum(log_weights, max);
    draw_from_weights(log_weights, uniform).ok_or(DrawFailure::Invalid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn find_cumulative_respects_boundaries_and_zero_weights() {
        let w = [0.0, 1.0, 0.0, 2.0, 0.0];
        assert_eq!(find_cumulative(&w, 0.0), 1);
        assert_eq!(find_cumulative(&w, 0.999), 1);
        assert_eq!(find_cumulative(&w, 1.0), 3);
        assert_eq!(find_cumulative(&w, 3.0), 3);
        let long: Vec<f64> = (0..37).map(|i| (i % 3) as f64).collect();
        let mut acc = 0.0;
        for (i, &w) in long.iter().enumerate() {
            if w > 0.0 {
                assert_eq!(find_cumulative(&long, acc + 0.5 * w), i);
            }
            acc += w;
        }
    }

    #[test]
    fn all_minus_infinity_is_degenerate() {
        let mut w = [0.0; 3];
        assert!(normalise_log_weights(&[f64::NEG_INFINITY; 3], &mut w).is_none());
        let mut l = [f64::NEG_INFINITY; 3];
        assert_eq!(
            draw_from_log_weights(&mut l, 0.5),
            Err(DrawFailure::Degenerate)
        );
        let mut bad = [0.0, f64::NAN];
        assert_eq!(
            draw_from_log_weights(&mut bad, 0.5),
            Err(DrawFailure::Invalid)
        );
        let mut inf = [0.0, f64::INFINITY];
        assert_eq!(
            draw_from_log_weights(&mut inf, 0.5),
            Err(DrawFailure::Invalid)
        );
    }

    #[test]
    fn ess_of_uniform_and_point_masses() {
        assert!((effective_sample_size(&[0.25; 4]) - 4.0).abs() < 1e-12);
        assert_eq!(effective_sample_size(&[0.0, 1.0, 0.0]), 1.0);
    }
}
