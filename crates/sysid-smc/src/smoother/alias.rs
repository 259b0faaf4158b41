//! Walker's alias table: O(1), branch-free draws from a categorical distribution.
//!
//! # Algorithm
//! Scale the weights to mean 1 and split the cells into *light* ones (`p < 1`, each
//! short of a whole cell by `d = 1 - p`) and *heavy* ones (`p >= 1`, each with an excess
//! `e = p - 1`), both in index order. The heavy cells fill the light cells' deficits
//! one after another, and a heavy cell whose excess is used up turns light itself and
//! is filled by the next heavy cell (the sweep of Hübschle-Schneider and Sanders, 2019).
//! With the running sums `D_k = d_0 + ... + d_k` (`D_-1 = 0`) and
//! `E_j = e_0 + ... + e_j`, the whole sweep follows from one merge of the two increasing
//! sequences:
//! * light cell `k` keeps `prob = p` and takes as alias the heavy cell
//!   `j(k) = min { j : E_j >= D_{k-1} }` that is filling when it comes;
//! * heavy cell `j` turns light at the first light cell `k` with `D_k > E_j`, keeping
//!   `prob = 1 + E_j - D_k` (at least 0: `D_k - E_j <= d_k <= 1`) with the next heavy
//!   cell as alias; one that never does, and the last one, keep their whole cell.
//!
//! Each heavy cell then gets `1 + e_j` in total (its own share, the deficits of the light
//! cells it fills and the rest of the previous heavy cell). The merge walks both sequences
//! with one comparison per step and no data-dependent branch: every step writes the
//! entries of both current cells, and the last write of each is the right one. Cells
//! left without a partner (all of them light, or the last heavy cell short) differ from a
//! whole cell only by rounding and keep it. A zero weight never gets probability: its
//! cell goes to its alias.
//!
//! (Vose's construction, a queue of small cells paired with the large ones, gives
//! another table for the same weights; on the reference machine it cost about 8 ns per
//! cell at M = 1000, against about 5 ns here: its chain runs through a store and a
//! reload of the large cell's remaining weight, and the compiler made branches of its
//! coin-toss tests.)
//!
//! A draw takes the cell `j = floor(u M)` of one uniform `u` and returns `j` if the
//! fraction `u M - j < prob[j]`, else `alias[j]`.
//!
//! # Complexity
//! O(M) to build (one pass to split and sum, one merge of at most `M` steps), O(1) per
//! draw (two loads and a select, no data-dependent branch).
//!
//! # References
//! Walker (1977); Vose, "A linear algorithm for generating random numbers with a given
//! distribution", IEEE TSE 17(9), 1991; Hübschle-Schneider and Sanders, "Parallel
//! weighted random sampling", ESA 2019.

use crate::weights::blocked_total;

/// An alias table over `M` non-negative weights with a positive total.
#[derive(Debug, Default)]
pub(crate) struct AliasTable {
    /// `M`.
    cells: usize,
    prob: Vec<f64>,
    alias: Vec<usize>,
    /// Light cells in index order, and `D_{k-1}` before each.
    light: Vec<usize>,
    deficit_before: Vec<f64>,
    /// Heavy cells in index order, and `E_j` of each.
    heavy: Vec<usize>,
    excess_through: Vec<f64>,
}

impl AliasTable {
    /// Rebuilds the table for `weights` (non-negative, positive finite total), reusing
    /// its buffers.
    pub fn build(&mut self, weights: &[f64]) {
        let m = weights.len();
        let scale = m as f64 / blocked_total(weights);
        self.cells = m;
        self.prob.resize(m, 0.0);
        // every cell's alias is written by the merge or after it; one scratch slot for
        // the merge's virtual last light cell
        self.alias.resize(m + 1, 0);
        self.light.resize(m + 1, 0);
        // (one more: the merge loads a step ahead)
        self.deficit_before.resize(m + 2, 0.0);
        self.heavy.resize(m + 1, 0);
        self.excess_through.resize(m + 1, 0.0);
        let mut light = LightCells {
            cells: &mut self.light,
            deficit_before: &mut self.deficit_before,
        };
        let mut heavy = HeavyCells {
            cells: &mut self.heavy,
            excess_through: &mut self.excess_through,
        };
        let (lights, heavies) =
            split_and_sum(weights, scale, &mut self.prob, &mut light, &mut heavy);
        merge(
            &mut self.prob,
            &mut self.alias,
            light,
            lights,
            heavy,
            heavies,
        );
    }

    /// The index drawn by the uniform `u` in [0, 1).
    #[inline(always)]
    pub fn draw(&self, u: f64) -> usize {
        let m = self.cells;
        let x = u * m as f64;
        let j = (x as usize).min(m - 1);
        let own = x - (j as f64) < self.prob[j];
        let alias = self.alias[j];
        // as a plain `if` (or a mask) the compiler makes a branch, which mispredicts
        // whenever the uniform's fraction is a coin toss
        std::hint::select_unpredictable(own, j, alias)
    }
}

/// Light cells in index order and `D_{k-1}` before each (slot `lights` is the
/// merge's virtual last cell).
struct LightCells<'a> {
    cells: &'a mut [usize],
    deficit_before: &'a mut [f64],
}

/// Heavy cells in index order and `E_j` of each.
struct HeavyCells<'a> {
    cells: &'a mut [usize],
    excess_through: &'a mut [f64],
}

/// Scales `weights` by `scale` into `prob` and splits the cells into light and heavy
/// ones with their running sums, without data-dependent branches (whether a cell is
/// light is a coin toss): both lists are written and one count advances. Sets the
/// virtual last light cell (index `M`, `D` at its total) and returns the counts.
fn split_and_sum(
    weights: &[f64],
    scale: f64,
    prob: &mut [f64],
    light_cells: &mut LightCells<'_>,
    heavy_cells: &mut HeavyCells<'_>,
) -> (usize, usize) {
    let (light, deficit_before) = (&mut *light_cells.cells, &mut *light_cells.deficit_before);
    let (heavy, excess_through) = (&mut *heavy_cells.cells, &mut *heavy_cells.excess_through);
    let (mut lights, mut heavies) = (0, 0);
    let (mut deficit, mut excess) = (0.0, 0.0);
    for (i, (&w, scaled)) in weights.iter().zip(prob.iter_mut()).enumerate() {
        let p = w * scale;
        *scaled = p;
        let is_light = p < 1.0;
        light[lights] = i;
        deficit_before[lights] = deficit;
        heavy[heavies] = i;
        // as `max`, not `if` (which the compiler turns into mispredicted branches)
        deficit += (1.0 - p).max(0.0);
        excess += (p - 1.0).max(0.0);
        excess_through[heavies] = excess;
        lights += usize::from(is_light);
        heavies += usize::from(!is_light);
    }
    light[lights] = weights.len();
    deficit_before[lights] = deficit;
    (lights, heavies)
}

/// The merge of the light cells' `D` with the heavy cells' `E`: writes `prob` of the
/// heavy cells and `alias` of all (see the module's algorithm). `alias` has a scratch
/// slot at index `M` for the virtual last light cell; `E` of the last heavy cell is
/// overwritten with `+inf` (it never turns light).
///
/// The loop-carried chain is a comparison and a select per step, with the candidates
/// after the current cells loaded a step ahead. `D` and `E` enter it as bit patterns:
/// the sums are non-negative and never -0 (they start at +0 and add `max(x, 0)`), and
/// non-negative doubles order as their bits do, so the chain runs in integer registers
/// with `cmov`. (As doubles, on the baseline instruction set without SSE4.1 blends,
/// each select became a branch that mispredicted at every coin-toss step; with the
/// filter's weights that cost about 3.5 us per table at M = 1000, the rejection FFBSi
/// benchmark's 21 ms against 17.5 ms now. Loading two steps ahead, so that no load
/// sits on the chain, measured no faster than one with the extra selects. Two
/// interleaved chains over the halves of the merge, each guarded against the other
/// half's cells, were slower than one.)
fn merge(
    prob: &mut [f64],
    alias: &mut [usize],
    light: LightCells<'_>,
    lights: usize,
    heavy: HeavyCells<'_>,
    heavies: usize,
) {
    if heavies == 0 {
        // every scaled weight is 1 up to rounding: whole cells
        for &l in &light.cells[..lights] {
            prob[l] = 1.0;
            alias[l] = l;
        }
        return;
    }
    // the last heavy cell fills to the end (if it ran out, only by rounding)
    heavy.excess_through[heavies - 1] = f64::INFINITY;
    let (d_of, e_of) = (&*light.deficit_before, &*heavy.excess_through);
    let (mut k, mut j) = (0, 0);
    // `d = D_{k-1}` and `e = E_j`, as bit patterns
    let (mut d, mut e) = (d_of[0].to_bits(), e_of[0].to_bits());
    // (`j < heavies` holds for finite weights: `E` of the last heavy cell is `+inf`)
    while k <= lights && j < heavies {
        let (l, h) = (light.cells[k], heavy.cells[j]);
        // light `k` is filled by `h` (final once `k` moves on)
        alias[l] = h;
        // heavy `j` turns light at the light cell before `k` (final once `j` moves on)
        prob[h] = (1.0 + f64::from_bits(e) - f64::from_bits(d)).max(0.0);
        alias[h] = heavy.cells[j + 1];
        let (d_next, e_next) = (d_of[k + 1].to_bits(), e_of[j + 1].to_bits());
        let heavy_done = e < d;
        j += usize::from(heavy_done);
        k += usize::from(!heavy_done);
        d = std::hint::select_unpredictable(heavy_done, d, d_next);
        e = std::hint::select_unpredictable(heavy_done, e_next, e);
    }
    // Heavy cells from `j` on never turned light (the current one was written
    // speculatively): whole cells.
    for &h in &heavy.cells[j..heavies] {
        prob[h] = 1.0;
        alias[h] = h;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The probability the table gives each index: its own share of its cell plus the
    /// shares of the cells that alias it, over `M`.
    fn table_probabilities(table: &AliasTable) -> Vec<f64> {
        let m = table.cells;
        let mut p = vec![0.0; m];
        for j in 0..m {
            p[j] += table.prob[j];
            p[table.alias[j]] += 1.0 - table.prob[j];
        }
        p.iter().map(|v| v / m as f64).collect()
    }

    #[test]
    fn the_table_reproduces_the_weights() {
        let mut table = AliasTable::default();
        use rand::RngExt;
        let mut rng = crate::stream(21, 0);
        let mut cases: Vec<Vec<f64>> = vec![
            vec![1.0],
            vec![0.0, 3.0, 0.0],
            vec![0.2, 0.3, 0.5],
            vec![0.1; 1000],
            vec![1e-300, 1.0, 1e-300],
            (0..1000)
                .map(|i| if i == 517 { 1e6 } else { 1.0 })
                .collect(),
            (0..1000).map(|i| ((i * 7919) % 113) as f64).collect(),
            (0..257)
                .map(|i| {
                    if i % 5 == 0 {
                        0.0
                    } else {
                        (-(i as f64) * 0.05).exp()
                    }
                })
                .collect(),
        ];
        // particle-filter-like weights: a few heavy, many light, a spread of scales
        for &spread in &[1.0, 10.0, 100.0] {
            for m in [2, 7, 64, 1000, 4096] {
                cases.push(
                    (0..m)
                        .map(|_| (-spread * rng.random::<f64>()).exp())
                        .collect(),
                );
            }
        }
        for weights in cases {
            table.build(&weights);
            let total: f64 = weights.iter().sum();
            for (i, (p, &w)) in table_probabilities(&table).iter().zip(&weights).enumerate() {
                assert!(
                    (p - w / total).abs() < 1e-13,
                    "M = {}, index {i}: {p} vs {}",
                    weights.len(),
                    w / total
                );
                if w == 0.0 {
                    assert_eq!(*p, 0.0, "a zero weight is never drawn (index {i})");
                }
            }
        }
    }

    #[test]
    fn draws_follow_the_cells() {
        let mut table = AliasTable::default();
        table.build(&[0.0, 1.0, 3.0]);
        // three cells of width 1/3: the uniform's cell and its fraction decide
        for k in 0..3000 {
            let u = (k as f64 + 0.5) / 3000.0;
            let j = (u * 3.0) as usize;
            let expected = if u * 3.0 - (j as f64) < table.prob[j] {
                j
            } else {
                table.alias[j]
            };
            let i = table.draw(u);
            assert_eq!(i, expected);
            assert_ne!(i, 0, "zero weight drawn at u = {u}");
        }
        let mut counts = [0usize; 3];
        for k in 0..3000 {
            counts[table.draw((k as f64 + 0.5) / 3000.0)] += 1;
        }
        assert_eq!(counts, [0, 750, 2250]);
    }
}
