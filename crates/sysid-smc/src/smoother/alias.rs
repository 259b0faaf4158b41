//! Walker's alias table: O(1), branch-free draws from a categorical distribution.
//!
//! # Algorithm
//! Vose's construction (1991): scale the weights to mean 1, then repeatedly pair an
//! entry below 1 (`small`, taken first in, first out) with one at or above 1
//! (`large`): the small entry keeps its
//! own probability `prob[s]` and gives the rest of its cell to `alias[s] = l`, whose
//! excess shrinks by `1 - prob[s]`. A draw takes the cell `j = floor(u M)` of one
//! uniform `u` and returns `j` if the fraction `u M - j < prob[j]`, else `alias[j]`.
//! Entries left when one list runs out differ from 1 only by rounding and keep their
//! whole cell. A zero weight never gets probability: its cell goes to its alias.
//!
//! # Complexity
//! O(M) to build, O(1) per draw (two loads and a select, no data-dependent branch).
//!
//! # References
//! Walker (1977); Vose, "A linear algorithm for generating random numbers with a given
//! distribution", IEEE TSE 17(9), 1991.

use crate::weights::blocked_total;

/// An alias table over `M` non-negative weights with a positive total.
#[derive(Debug, Default)]
pub(crate) struct AliasTable {
    prob: Vec<f64>,
    alias: Vec<usize>,
    scaled: Vec<f64>,
    small: Vec<usize>,
    large: Vec<usize>,
}

impl AliasTable {
    /// Rebuilds the table for `weights` (non-negative, positive finite total), reusing
    /// its buffers.
    pub fn build(&mut self, weights: &[f64]) {
        let m = weights.len();
        let scale = m as f64 / blocked_total(weights);
        self.scaled.clear();
        self.scaled.extend(weights.iter().map(|&w| w * scale));
        self.prob.clear();
        self.prob.resize(m, 1.0);
        self.alias.clear();
        self.alias.extend(0..m);
        // Without data-dependent branches (whether an entry is small is a coin toss):
        // partition into `small` and `large` by writing both and advancing one count,
        // then pair them with `small` as a queue that grows at its end.
        self.small.resize(m, 0);
        self.large.resize(m, 0);
        let (mut small_len, mut large_len) = (0, 0);
        for (i, &p) in self.scaled.iter().enumerate() {
            let is_small = p < 1.0;
            self.small[small_len] = i;
            self.large[large_len] = i;
            small_len += usize::from(is_small);
            large_len += usize::from(!is_small);
        }
        let (mut next_small, mut next_large) = (0, 0);
        while next_small < small_len && next_large < large_len {
            let s = self.small[next_small];
            let l = self.large[next_large];
            next_small += 1;
            self.prob[s] = self.scaled[s];
            self.alias[s] = l;
            let rest = (self.scaled[l] + self.scaled[s]) - 1.0;
            self.scaled[l] = rest;
            // `l` turns small: it joins the queue and leaves the large list
            let turns_small = rest < 1.0;
            self.small[small_len] = l;
            small_len += usize::from(turns_small);
            next_large += usize::from(turns_small);
        }
        // what is left differs from 1 only by rounding: whole cells (prob stays 1)
    }

    /// The index drawn by the uniform `u` in [0, 1).
    #[inline(always)]
    pub fn draw(&self, u: f64) -> usize {
        let m = self.prob.len();
        let x = u * m as f64;
        let j = (x as usize).min(m - 1);
        let own = x - (j as f64) < self.prob[j];
        let alias = self.alias[j];
        if own { j } else { alias }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The probability the table gives each index: its own share of its cell plus the
    /// shares of the cells that alias it, over `M`.
    fn table_probabilities(table: &AliasTable) -> Vec<f64> {
        let m = table.prob.len();
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
        let cases: Vec<Vec<f64>> = vec![
            vec![1.0],
            vec![0.0, 3.0, 0.0],
            vec![0.2, 0.3, 0.5],
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
        for weights in cases {
            table.build(&weights);
            let total: f64 = weights.iter().sum();
            for (i, (p, &w)) in table_probabilities(&table).iter().zip(&weights).enumerate() {
                assert!(
                    (p - w / total).abs() < 1e-13,
                    "index {i}: {p} vs {}",
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
