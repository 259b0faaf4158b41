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
//! however the blocks are shared out. Inside a block the running sum goes by groups of
//! eight: `L_i = K_j + (w_{8j} + ... + w_i)` with the carry `K_{j+1} = K_j + (w_{8j} +
//! ... + w_{8j+7})`, so that one addition per group, not per particle, waits for the
//! previous one. The total is the sum of the blocks' eight-element block sums.
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

/// [`systematic`] with running sums in blocks of `block <= BLOCK` particles: the
/// blocks of [`plan_blocks`] and [`mark_block`] one after another, each block's running
/// sums on the stack.
#[inline(always)]
pub(crate) fn systematic_in_blocks(weights: &[f64], u: f64, out: &mut [usize], block: usize) {
    assert!(block <= BLOCK, "blocks of at most BLOCK particles");
    let total = weights
        .chunks(block)
        .map(blocked_total)
        .reduce(|a, b| a + b);
    let marks = Marks::new(out.len(), total.unwrap_or(0.0), u);
    let last = last_positive(weights);
    if weights.is_empty() {
        out.fill(0);
        return;
    }
    // (the blocks' slot ranges cover every output: the first starts at 0, each ends
    // where the next starts, the last one at the end)
    let mut running = [0.0; BLOCK];
    let mut plan = BlockPlan::default();
    for (b, chunk) in weights.chunks(block).enumerate() {
        let first = b * block;
        if b > 0 && first >= last {
            break; // the block before took the slots up to the end
        }
        let running = &mut running[..chunk.len()];
        let next_offset = plan.offset + block_running_sums(chunk, running).end;
        plan.end_slot = first_slot(weights, b + 1, block, next_offset, last, &marks);
        let slots = &mut out[plan.first_slot..plan.end_slot];
        mark_block(running, first, last, &plan, &marks, slots);
        plan = BlockPlan {
            offset: next_offset,
            first_slot: plan.end_slot,
            end_slot: 0,
        };
    }
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
    let mut carry = 0.0;
    for (group, sums) in weights.chunks(GROUP).zip(running.chunks_mut(GROUP)) {
        carry = group_running_sums(group, carry, sums);
    }
    BlockSums {
        end: carry,
        total: blocked_total(weights),
    }
}

/// Weights per group of a block's running sums.
const GROUP: usize = 8;

/// The running sums of one group: `carry` plus the plain running sum of the group
/// from zero. Returns the last (the next group's carry). Only that one addition waits
/// for the previous group, so the additions of neighbouring groups overlap instead of
/// forming one chain through the block.
#[inline(always)]
fn group_running_sums(group: &[f64], carry: f64, sums: &mut [f64]) -> f64 {
    let mut local = 0.0;
    for (sum, &w) in sums.iter_mut().zip(group) {
        local += w;
        *sum = carry + local;
    }
    carry + local
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
    /// The rule for `outputs` positions (fewer than 2^52), the weights' `total` and
    /// the uniform `u`.
    #[inline(always)]
    pub fn new(outputs: usize, total: f64, u: f64) -> Self {
        debug_assert!(outputs < 1 << 52);
        Marks {
            outputs,
            scale: outputs as f64 / total,
            u,
        }
    }

    /// The number of positions below the cumulative weight `cumulative` (0 for NaN).
    ///
    /// Branch-free, so that a block of counts is computed with vector instructions
    /// (`ceil` is one instruction from SSE 4.1 on; see [`small_integer`]).
    #[inline(always)]
    pub fn count(&self, cumulative: f64) -> usize {
        let z = (cumulative * self.scale - self.u).ceil();
        let low = if z > 0.0 { z } else { 0.0 }; // NaN -> 0
        let outputs = self.outputs as f64;
        small_integer(if low < outputs { low } else { outputs })
    }
}

/// The value of a whole number `0 <= v < 2^52` held as a float, without the range
/// and NaN checks of `as`, which keep a conversion from being vectorised: adding 2^52
/// puts `v` into the low bits of the mantissa exactly.
#[inline(always)]
fn small_integer(v: f64) -> usize {
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    ((v + TWO_52).to_bits() - TWO_52.to_bits()) as usize
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
    sums: impl Iterator<Item = BlockSums> + Clone,
    block: usize,
    u: f64,
    outputs: usize,
    last: usize,
    plan: &mut Vec<BlockPlan>,
) -> Marks {
    let total = sums.clone().map(|s| s.total).reduce(|a, b| a + b);
    let marks = Marks::new(outputs, total.unwrap_or(0.0), u);
    plan.clear();
    let mut offset = 0.0;
    for (b, sums) in sums.enumerate() {
        plan.push(BlockPlan {
            offset,
            first_slot: first_slot(weights, b, block, offset, last, &marks),
            end_slot: outputs,
        });
        offset += sums.end;
    }
    for b in 1..plan.len() {
        plan[b - 1].end_slot = plan[b].first_slot;
    }
    marks
}

/// The first output slot of block `b` with running-sum offset `offset`: 0 for the
/// first block, the count of its first particle (`L_first = 0 + w_first = w_first`)
/// while that is below `last`, else past the end (the block writes nothing).
#[inline(always)]
fn first_slot(
    weights: &[f64],
    b: usize,
    block: usize,
    offset: f64,
    last: usize,
    marks: &Marks,
) -> usize {
    let first = b * block;
    if b == 0 {
        0
    } else if first < last {
        marks.count(offset + weights[first])
    } else {
        marks.outputs
    }
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
    let mut counts = [0usize; COUNT_GROUP];
    for (g, group) in running[..end].chunks(COUNT_GROUP).enumerate() {
        // the counts first (vectorised), then the scattered marks
        for (count, &local) in counts.iter_mut().zip(group) {
            *count = marks.count(plan.offset + local);
        }
        for (k, &count) in counts[..group.len()].iter().enumerate() {
            // (a slot below the range is impossible for finite weights, whose counts
            // grow; the wrapping check keeps NaN weights from writing out of range)
            let slot = count.wrapping_sub(plan.first_slot);
            if slot < out.len() {
                out[slot] = first + g * COUNT_GROUP + k + 1;
            }
        }
    }
    running_max(out);
}

/// Counts computed together before their marks are stored.
const COUNT_GROUP: usize = 32;

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
    /// operations: running sums by groups of eight, restarted every `block` particles).
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
            let mut carry = 0.0; // K_j
            for group in chunk.chunks(8) {
                let mut partial = 0.0;
                for &w in group {
                    partial += w;
                    counts.push(marks.count(offset + (carry + partial)));
                }
                carry += partial;
            }
            offset += carry;
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
        let marks = plan_blocks(weights, sums.iter().copied(), block, u, n, last, &mut plan);
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
            let block = 1 + case % 23;
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
    fn small_integers_convert_exactly() {
        for v in [0usize, 1, 2, 1023, 1 << 30, (1 << 52) - 1] {
            assert_eq!(small_integer(v as f64), v);
        }
        let marks = Marks::new(10, 1.0, 0.5);
        assert_eq!(marks.count(f64::NAN), 0);
        assert_eq!(marks.count(-3.0), 0);
        assert_eq!(marks.count(0.25), 2); // ceil(2.5 - 0.5) = 2
        assert_eq!(marks.count(0.26), 3); // ceil(2.1) = 3
        assert_eq!(marks.count(7.0), 10);
        assert_eq!(marks.count(f64::INFINITY), 10);
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
