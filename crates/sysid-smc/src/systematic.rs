//! Systematic resampling, organised in blocks so that a team of threads can share it.
//!
//! # Algorithm
//! With `N` outputs and the single uniform `u` in [0, 1), position `k` is `(k + u) / N`
//! of the total weight. The ancestor of position `k` is the number of particles `i`
//! (below the last one with positive weight) whose count `ceil(N C_i / total - u)` is at
//! most `k`, where `C_i` is the cumulative weight. Counts grow with `i`, so each count
//! is marked with `i + 1` (the last mark of a slot wins) and a running maximum fills
//! the slots in between. Plain stores, no data-dependent branches.
//!
//! The cumulative weights are formed in blocks of [`BLOCK`] particles: a running sum
//! `L_i` inside each block, and block offsets `O_{b+1} = O_b + L_end(b)`, so that
//! `C_i = O_b + L_i`. The block running sums are independent, which lets every block
//! be summed and marked by a different thread; the result (integers) is the same
//! however the blocks are shared out. With at most one block (M <= [`BLOCK`]) this is
//! the plain running sum. The total is the sum of the blocks' eight-element block sums.
//!
//! # Complexity
//! O(M + N) time, no allocation.

use crate::weights::blocked_total;

/// Particles per block of running sums (the particle filter's chunk).
pub const BLOCK: usize = 1024;

/// Systematic resampling of `weights` (non-negative, any scale) into `out`.
#[inline(always)]
pub fn systematic(weights: &[f64], u: f64, out: &mut [usize]) {
    systematic_in_blocks(weights, u, out, BLOCK);
}

/// [`systematic`] with running sums in blocks of `block` particles.
#[inline(always)]
pub(crate) fn systematic_in_blocks(weights: &[f64], u: f64, out: &mut [usize], block: usize) {
    let total: f64 = weights
        .chunks(block)
        .map(blocked_total)
        .reduce(|a, b| a + b)
        .unwrap_or(0.0);
    let marks = Marks::new(out.len(), total, u);
    let last = last_positive(weights);
    out.fill(0);
    let mut offset = 0.0;
    for (b, chunk) in weights[..last].chunks(block).enumerate() {
        let mut local = 0.0;
        for (k, &w) in chunk.iter().enumerate() {
            local += w;
            let count = marks.count(offset + local);
            if count < out.len() {
                out[count] = b * block + k + 1;
            }
        }
        offset += local;
    }
    running_max(out);
}

/// The index after which every weight is zero (0 when at most the first is positive):
/// particles from it on are never marked.
#[inline(always)]
pub(crate) fn last_positive(weights: &[f64]) -> usize {
    weights.iter().rposition(|&w| w > 0.0).unwrap_or(0)
}

/// The running sums of one block: writes `L_i` into `running` and returns the block's
/// end `L_end` and its total as eight-element block sums.
#[inline(always)]
pub(crate) fn block_running_sums(weights: &[f64], running: &mut [f64]) -> BlockSums {
    let mut local = 0.0;
    for (r, &w) in running.iter_mut().zip(weights) {
        local += w;
        *r = local;
    }
    BlockSums {
        end: local,
        total: blocked_total(weights),
    }
}

/// What [`block_running_sums`] reports of a block.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct BlockSums {
    /// The block's last running sum `L_end`.
    pub end: f64,
    /// The block's total, as eight-element block sums.
    pub total: f64,
}

/// The counting rule `count = ceil(C N / total - u)`, clamped to `[0, N]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Marks {
    outputs: usize,
    scale: f64,
    u: f64,
}

impl Marks {
    /// The rule for `outputs` positions, the weights' `total` and the uniform `u`.
    #[inline(always)]
    pub fn new(outputs: usize, total: f64, u: f64) -> Self {
        Marks {
            outputs,
            scale: outputs as f64 / total,
            u,
        }
    }

    /// The number of positions below the cumulative weight `cumulative`.
    #[inline(always)]
    pub fn count(&self, cumulative: f64) -> usize {
        // ceil without a libm call: truncate, then add one if something was cut off
        let z = cumulative * self.scale - self.u;
        let truncated = z as i64;
        (truncated + i64::from((truncated as f64) < z)).clamp(0, self.outputs as i64) as usize
    }
}

/// Where one block of particles writes its ancestors: the output slots
/// `[first_slot, end_slot)`, and the offset `O_b` of its running sums. The blocks'
/// slot ranges partition the outputs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct BlockPlan {
    pub offset: f64,
    pub first_slot: usize,
    pub end_slot: usize,
}

/// Plans the blocks from their sums (in block order): fills `plan` (one entry per
/// block) and returns the counting rule. `weights` are all the weights and `last`
/// their [`last_positive`] index.
///
/// Block `b > 0` starts at the count of its first particle, which it always marks, so
/// a running maximum started afresh inside its range is the global one; a block whose
/// first particle is at or past `last` writes nothing, and the last block that writes
/// takes the slots up to the end.
pub(crate) fn plan_blocks(
    weights: &[f64],
    sums: &[BlockSums],
    block: usize,
    u: f64,
    outputs: usize,
    last: usize,
    plan: &mut Vec<BlockPlan>,
) -> Marks {
    let total = sums.iter().map(|s| s.total).reduce(|a, b| a + b);
    let marks = Marks::new(outputs, total.unwrap_or(0.0), u);
    plan.clear();
    let mut offset = 0.0;
    for (b, sums) in sums.iter().enumerate() {
        let first = b * block;
        let first_slot = if b == 0 {
            0
        } else if first < last {
            // L_first = 0 + w_first = w_first
            marks.count(offset + weights[first])
        } else {
            outputs
        };
        plan.push(BlockPlan {
            offset,
            first_slot,
            end_slot: outputs,
        });
        offset += sums.end;
    }
    for b in 1..plan.len() {
        plan[b - 1].end_slot = plan[b].first_slot;
    }
    marks
}

/// Writes the ancestors of one block's slots `out = [first_slot, end_slot)` from its
/// running sums (`running`, for particles `first..`), marking only particles below
/// `last`.
#[inline(always)]
pub(crate) fn mark_block(
    running: &[f64],
    first: usize,
    last: usize,
    plan: &BlockPlan,
    marks: &Marks,
    out: &mut [usize],
) {
    out.fill(0);
    let end = last.saturating_sub(first).min(running.len());
    for (k, &local) in running[..end].iter().enumerate() {
        // (a slot below the range is impossible for finite weights, whose counts
        // grow; the wrapping check keeps NaN weights from writing out of range)
        let slot = marks
            .count(plan.offset + local)
            .wrapping_sub(plan.first_slot);
        if slot < out.len() {
            out[slot] = first + k + 1;
        }
    }
    running_max(out);
}

/// Replaces each entry by the largest entry up to it.
#[inline(always)]
fn running_max(out: &mut [usize]) {
    let mut running = 0;
    for slot in out.iter_mut() {
        running = running.max(*slot);
        *slot = running;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streams::stream;
    use rand::RngExt;

    /// Systematic resampling by its definition: position `k` goes to the number of
    /// particles `i < last` whose count is at most `k` (O(n M), the same floating-point
    /// operations, with the running sums restarted every `block` particles).
    fn by_definition(weights: &[f64], u: f64, n: usize, block: usize) -> Vec<usize> {
        let total = weights
            .chunks(block)
            .map(blocked_total)
            .reduce(|a, b| a + b)
            .unwrap();
        let marks = Marks::new(n, total, u);
        let last = last_positive(weights);
        let mut counts = Vec::new();
        let mut offset = 0.0;
        for chunk in weights.chunks(block) {
            let mut local = 0.0;
            for &w in chunk {
                local += w;
                counts.push(marks.count(offset + local));
            }
            offset += local;
        }
        counts.truncate(last);
        (0..n)
            .map(|k| counts.iter().filter(|&&c| c <= k).count())
            .collect()
    }

    /// The blocks worked one by one through the plan, as a team of threads works them.
    fn by_blocks(weights: &[f64], u: f64, n: usize, block: usize) -> Vec<usize> {
        let mut running = vec![0.0; weights.len()];
        let sums: Vec<BlockSums> = weights
            .chunks(block)
            .zip(running.chunks_mut(block))
            .map(|(w, r)| block_running_sums(w, r))
            .collect();
        let last = last_positive(weights);
        let mut plan = Vec::new();
        let marks = plan_blocks(weights, &sums, block, u, n, last, &mut plan);
        let mut out = vec![usize::MAX; n];
        for (b, p) in plan.iter().enumerate() {
            assert!(p.first_slot <= p.end_slot);
            let first = b * block;
            mark_block(
                &running[first..(first + block).min(weights.len())],
                first,
                last,
                p,
                &marks,
                &mut out[p.first_slot..p.end_slot],
            );
        }
        out
    }

    fn random_weights(case: usize, m: usize, rng: &mut crate::Rng) -> Vec<f64> {
        (0..m)
            .map(|i| match (case + i) % 7 {
                0 => 0.0,
                1 => 30.0 * rng.random::<f64>(), // long runs of one ancestor
                2 if case.is_multiple_of(3) => 0.0,
                _ => rng.random::<f64>(),
            })
            .collect()
    }

    #[test]
    fn single_pass_and_blocks_equal_the_definition() {
        let mut rng = stream(11, 0);
        for case in 0..600 {
            let m = 1 + case % 37;
            let n = 1 + (case * 7) % 41;
            let block = 1 + case % 9;
            let mut weights = random_weights(case, m, &mut rng);
            if case.is_multiple_of(11) {
                // zero tails: blocks past the last positive weight write nothing
                let keep = m / 3;
                weights[keep..].fill(0.0);
            }
            if weights.iter().all(|&w| w == 0.0) {
                continue;
            }
            let u = rng.random::<f64>();
            let expected = by_definition(&weights, u, n, block);
            let mut out = vec![usize::MAX; n];
            systematic_in_blocks(&weights, u, &mut out, block);
            assert_eq!(out, expected, "single pass, case {case}");
            assert_eq!(
                by_blocks(&weights, u, n, block),
                expected,
                "blocks, case {case}"
            );
        }
    }

    #[test]
    fn one_block_is_the_plain_running_sum() {
        let mut rng = stream(12, 0);
        for case in 0..100 {
            let weights = random_weights(case, 1 + case % 50, &mut rng);
            if weights.iter().all(|&w| w == 0.0) {
                continue;
            }
            let u = rng.random::<f64>();
            let n = 1 + case % 23;
            let mut one = vec![0; n];
            systematic_in_blocks(&weights, u, &mut one, 64);
            let mut whole = vec![0; n];
            systematic_in_blocks(&weights, u, &mut whole, usize::MAX);
            assert_eq!(one, whole, "case {case}");
        }
    }

    #[test]
    fn a_point_mass_takes_every_slot() {
        for at in 0..12 {
            let mut w = vec![0.0; 12];
            w[at] = 2.5;
            for block in [1, 4, 5, 12] {
                assert_eq!(by_blocks(&w, 0.3, 7, block), vec![at; 7]);
            }
        }
    }
}
