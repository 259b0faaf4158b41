//! Capped rejection sampling for a block of rows, in rounds.
//!
//! # Algorithm
//! Row `k` proposes a candidate `i` and accepts it with probability
//! `exp(log_ratio(k, i)) <= 1`, tested as `log_ratio(k, i) > -E` with `E ~ Exp(1)` (no
//! exponential). A round gives every row still open one trial; the accepted rows leave
//! the open list by an index increment instead of a branch, since whether a trial is
//! accepted is a coin toss that a branch predictor cannot learn (one misprediction per
//! trial cost more than the trial itself). After `trials` rounds the rows still open
//! are left to the caller's exact draw, which keeps every row's draw exact: a row's
//! trials use fresh random numbers whatever the other rows do, and the exact draw after
//! a run of rejections has the target distribution too.
//!
//! The trials' numbers (a uniform for the proposal, an exponential for the test) come
//! in bulk from [`TrialNumbers`], one run of pairs per round (the open rows in row
//! order), so the draws depend only on the block's stream.
//!
//! # Complexity
//! One proposal, one `log_ratio` and one bulk pair of random numbers per trial,
//! branch-free.

use super::backward::PATH_BLOCK;
use crate::streams::Rng;
use crate::trial_numbers::TrialNumbers;

// a round takes one run of trial numbers for a whole block, and rows are kept as `u8`
const _: () = assert!(PATH_BLOCK <= crate::trial_numbers::CHUNK && PATH_BLOCK <= 256);

/// What [`draw_in_rounds`] leaves open: the rows that rejected every trial.
pub(crate) struct OpenRows {
    rows: [u8; PATH_BLOCK],
    len: usize,
    /// Trials made, over all rows.
    pub trials: u64,
}

impl OpenRows {
    /// The rows that rejected every trial, in row order.
    pub fn rows(&self) -> impl Iterator<Item = usize> + '_ {
        self.rows[..self.len].iter().map(|&k| usize::from(k))
    }
}

/// Up to `trials` rejection trials for each of the `chosen.len() <= PATH_BLOCK` rows:
/// candidates from `propose` (given the row and a uniform in [0, 1)), accepted with probability
/// `exp(log_ratio(row, candidate))`, into `chosen[row]`. Returns the rows left open
/// (their `chosen` entries are the last rejected candidates, for the caller to
/// overwrite).
#[inline(always)]
pub(crate) fn draw_in_rounds(
    trials: usize,
    rng: &mut Rng,
    propose: impl Fn(usize, f64) -> usize,
    mut log_ratio: impl FnMut(usize, usize) -> f64,
    chosen: &mut [usize],
) -> OpenRows {
    let rows = chosen.len();
    debug_assert!(rows <= PATH_BLOCK, "a block has at most PATH_BLOCK rows");
    let mut open = OpenRows {
        rows: [0; PATH_BLOCK],
        len: rows,
        trials: 0,
    };
    for (k, slot) in open.rows[..rows].iter_mut().enumerate() {
        *slot = k as u8;
    }
    let mut numbers = TrialNumbers::new();
    let mut candidates = [0usize; PATH_BLOCK];
    let mut accepted = [false; PATH_BLOCK];
    for _ in 0..trials {
        let len = open.len;
        if len == 0 {
            break;
        }
        open.trials += len as u64;
        // Three passes over the open rows: the proposals, the tests, then the
        // compaction of the rows still open. The first two have no loop-carried
        // dependency, and no trial's whole chain (proposal, density, test) sits on the
        // count of open rows.
        let (uniforms, exponentials) = numbers.take(rng, len);
        for ((candidate, &u), &k) in candidates[..len].iter_mut().zip(uniforms).zip(&open.rows) {
            *candidate = propose(usize::from(k), u);
        }
        for j in 0..len {
            let k = usize::from(open.rows[j]);
            accepted[j] = log_ratio(k, candidates[j]) > -exponentials[j];
        }
        let mut still_open = 0;
        for j in 0..len {
            let k = usize::from(open.rows[j]);
            chosen[k] = candidates[j];
            open.rows[still_open] = k as u8;
            still_open += usize::from(!accepted[j]);
        }
        open.len = still_open;
    }
    open
}

/// A uniform candidate among `m` from a uniform in [0, 1).
#[inline(always)]
pub(crate) fn uniform_index(uniform: f64, m: usize) -> usize {
    ((uniform * m as f64) as usize).min(m - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streams::stream;

    /// Rows with acceptance probabilities `p_k(i)`: the accepted candidates and the
    /// open rows follow from the trials' own random numbers, replayed here one trial
    /// at a time in the documented order.
    #[test]
    fn rounds_replay_the_documented_order() {
        let m = 7;
        let rows = 20;
        let log_ratio = |k: usize, i: usize| ((k * 3 + i) % 5) as f64 * -0.7;
        let mut drawn = vec![usize::MAX; rows];
        let rounds = draw_in_rounds(
            3,
            &mut stream(5, 1),
            |_, u| uniform_index(u, m),
            log_ratio,
            &mut drawn,
        );
        let mut rng = stream(5, 1);
        let mut numbers = TrialNumbers::new();
        let mut open: Vec<usize> = (0..rows).collect();
        let mut chosen = vec![usize::MAX; rows];
        let mut trials = 0;
        for _ in 0..3 {
            let mut next = Vec::new();
            let (uniforms, exponentials) = numbers.take(&mut rng, open.len());
            for (j, &k) in open.iter().enumerate() {
                trials += 1;
                let i = uniform_index(uniforms[j], m);
                chosen[k] = i;
                if log_ratio(k, i) <= -exponentials[j] {
                    next.push(k);
                }
            }
            open = next;
        }
        assert_eq!(rounds.trials, trials);
        assert_eq!(rounds.rows().collect::<Vec<_>>(), open);
        assert!(!open.is_empty() && open.len() < rows, "both outcomes occur");
        for k in (0..rows).filter(|k| !open.contains(k)) {
            assert_eq!(drawn[k], chosen[k], "row {k}");
        }
    }

    /// An accepted candidate has the target distribution `∝ exp(log_ratio)`: with
    /// unlimited trials, the frequencies match within 4 binomial standard errors.
    #[test]
    fn accepted_candidates_follow_the_target() {
        let m = 5;
        let ratio = [1.0, 0.5, 0.25, 0.1, 0.05];
        let total: f64 = ratio.iter().sum();
        let mut counts = [0usize; 5];
        let mut draws = 0;
        for block in 0..2000 {
            let mut drawn = [0; PATH_BLOCK];
            let open = draw_in_rounds(
                10_000,
                &mut stream(9, block),
                |_, u| uniform_index(u, m),
                |_, i| f64::ln(ratio[i]),
                &mut drawn,
            );
            assert_eq!(open.rows().count(), 0);
            for &i in &drawn {
                counts[i] += 1;
                draws += 1;
            }
        }
        for (i, &c) in counts.iter().enumerate() {
            let p = ratio[i] / total;
            let se = (p * (1.0 - p) / draws as f64).sqrt();
            let freq = c as f64 / draws as f64;
            assert!((freq - p).abs() < 4.0 * se, "candidate {i}: {freq} vs {p}");
        }
    }
}
