//! The per-step sums over smoothed paths that affine EM's statistics are made of.
//!
//! # Algorithm
//! For `k` columns `c_0 .. c_{k-1}` of one value per path, [`PathMoments::sum`] forms
//! `S_ij = sum_p c_i[p] c_j[p]` (`i <= j`) and `s_i = sum_p c_i[p]` in one pass over
//! the paths, eight paths at a time: every sum has its own eight-lane accumulator, so
//! the pass is bound by the multiply-adds' throughput rather than by one long chain of
//! additions per sum. The last paths of a partial block are padded with zeros. Each
//! accumulator's lanes are added in a fixed tree, so the result depends only on the
//! columns.
//!
//! # Complexity
//! `k (k + 3) / 2` vector multiply-adds per eight paths.

/// Paths per block: one AVX-512 vector.
const LANES: usize = 8;

/// Eight lanes on one cache line (a vector load or store never straddles two).
#[derive(Debug, Clone, Copy, Default)]
#[repr(align(64))]
struct Lanes([f64; LANES]);

/// Reusable accumulators of [`PathMoments::sum`].
#[derive(Debug, Clone, Default)]
pub(crate) struct PathMoments {
    /// The current block of eight paths, by column.
    block: Vec<Lanes>,
    products: Vec<Lanes>,
    sums: Vec<Lanes>,
}

impl PathMoments {
    /// For the `k` columns of `paths` entries each in `columns` (column `i` at
    /// `columns[i * paths..]`): `products[j * k + i] = S_ij` for `i <= j` (the entries
    /// below the diagonal are left as they are) and `sums[i] = s_i`.
    #[inline(always)]
    pub fn sum(
        &mut self,
        columns: &[f64],
        paths: usize,
        k: usize,
        products: &mut [f64],
        sums: &mut [f64],
    ) {
        debug_assert!(columns.len() >= k * paths && products.len() >= k * k);
        // up to six columns the accumulators live in registers
        match k {
            1 => sum_in_registers::<1>(columns, paths, products, sums),
            2 => sum_in_registers::<2>(columns, paths, products, sums),
            3 => sum_in_registers::<3>(columns, paths, products, sums),
            4 => sum_in_registers::<4>(columns, paths, products, sums),
            5 => sum_in_registers::<5>(columns, paths, products, sums),
            6 => sum_in_registers::<6>(columns, paths, products, sums),
            _ => self.sum_in_memory(columns, paths, k, products, sums),
        }
    }

    /// [`Self::sum`] for any `k`, with the accumulators in `self`.
    #[inline(always)]
    fn sum_in_memory(
        &mut self,
        columns: &[f64],
        paths: usize,
        k: usize,
        products: &mut [f64],
        sums: &mut [f64],
    ) {
        self.products.clear();
        self.products.resize(k * k, Lanes::default());
        self.sums.clear();
        self.sums.resize(k, Lanes::default());
        self.block.resize(k, Lanes::default());
        for first in (0..paths).step_by(LANES) {
            load_block(columns, paths, first, &mut self.block);
            accumulate_block(&self.block, &mut self.products, &mut self.sums);
        }
        write_totals(&self.products, &self.sums, products, sums);
    }
}

/// [`PathMoments::sum`] for `K` columns, with the accumulators in local arrays.
#[inline(always)]
fn sum_in_registers<const K: usize>(
    columns: &[f64],
    paths: usize,
    products: &mut [f64],
    sums: &mut [f64],
) {
    let mut block = [Lanes::default(); K];
    let mut product_lanes = [[Lanes::default(); K]; K];
    let mut sum_lanes = [Lanes::default(); K];
    for first in (0..paths).step_by(LANES) {
        load_block(columns, paths, first, &mut block);
        accumulate_block(&block, product_lanes.as_flattened_mut(), &mut sum_lanes);
    }
    write_totals(product_lanes.as_flattened(), &sum_lanes, products, sums);
}

/// Paths `first..first + 8` of each column into `block` (zeros past the last path).
#[inline(always)]
fn load_block(columns: &[f64], paths: usize, first: usize, block: &mut [Lanes]) {
    let len = LANES.min(paths - first);
    for (i, lanes) in block.iter_mut().enumerate() {
        let values = &columns[i * paths + first..];
        if len == LANES {
            lanes.0.copy_from_slice(&values[..LANES]);
        } else {
            // element by element: a library copy call would spill the accumulators
            for (l, lane) in lanes.0.iter_mut().enumerate() {
                *lane = if l < len { values[l] } else { 0.0 };
            }
        }
    }
}

/// Adds a block's products `c_i c_j` (`i <= j`, at `j * k + i`) and values `c_j` to
/// the lane accumulators.
#[inline(always)]
fn accumulate_block(block: &[Lanes], products: &mut [Lanes], sums: &mut [Lanes]) {
    let k = block.len();
    for (j, cj) in block.iter().enumerate() {
        for (i, ci) in block[..=j].iter().enumerate() {
            let acc = &mut products[j * k + i];
            acc.0 = multiply_add(acc.0, ci.0, cj.0);
        }
        sums[j].0 = multiply_add(sums[j].0, cj.0, [1.0; LANES]);
    }
}

/// The accumulators' lane totals into `products` (upper triangle) and `sums`.
#[inline(always)]
fn write_totals(
    product_lanes: &[Lanes],
    sum_lanes: &[Lanes],
    products: &mut [f64],
    sums: &mut [f64],
) {
    let k = sum_lanes.len();
    for j in 0..k {
        for i in 0..=j {
            products[j * k + i] = lane_total(&product_lanes[j * k + i].0);
        }
        sums[j] = lane_total(&sum_lanes[j].0);
    }
}

/// `acc + a b`, lane by lane (one vector multiply and add).
#[inline(always)]
fn multiply_add(mut acc: [f64; LANES], a: [f64; LANES], b: [f64; LANES]) -> [f64; LANES] {
    for l in 0..LANES {
        acc[l] += a[l] * b[l];
    }
    acc
}

/// The lanes of an accumulator added in a fixed tree.
#[inline(always)]
fn lane_total(a: &[f64; LANES]) -> f64 {
    ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against plain sums, for path counts around the block size and a few column
    /// counts; the values are small integers times 1/4, so every sum is exact in any
    /// order and the comparison is bit for bit.
    #[test]
    fn sums_equal_plain_sums_for_any_path_count() {
        for paths in [1, 7, 8, 9, 16, 50] {
            for k in [1, 3, 5, 7] {
                let columns: Vec<f64> = (0..k * paths)
                    .map(|v| ((v * 37 % 23) as f64 - 11.0) * 0.25)
                    .collect();
                let column = |i: usize| &columns[i * paths..(i + 1) * paths];
                let mut products = vec![f64::NAN; k * k];
                let mut sums = vec![0.0; k];
                PathMoments::default().sum(&columns, paths, k, &mut products, &mut sums);
                for j in 0..k {
                    for i in 0..=j {
                        let plain: f64 = column(i).iter().zip(column(j)).map(|(a, b)| a * b).sum();
                        assert_eq!(products[j * k + i], plain, "{paths} paths, S_{i}{j}");
                    }
                    for i in j + 1..k {
                        assert!(products[j * k + i].is_nan(), "below the diagonal untouched");
                    }
                    assert_eq!(sums[j], column(j).iter().sum::<f64>(), "s_{j}");
                }
            }
        }
    }

    /// The register path (up to six columns) and the general one add the same numbers
    /// in the same order: equal bit for bit on values whose sums round.
    #[test]
    fn register_and_memory_paths_agree_bit_for_bit() {
        let paths = 53;
        for k in 1..=6 {
            let columns: Vec<f64> = (0..k * paths)
                .map(|v| (v as f64 * 0.7131).sin() * 3.7 + 1.0 / (v as f64 + 1.3))
                .collect();
            let (mut p_reg, mut s_reg) = (vec![0.0; k * k], vec![0.0; k]);
            let (mut p_mem, mut s_mem) = (vec![0.0; k * k], vec![0.0; k]);
            let mut moments = PathMoments::default();
            moments.sum(&columns, paths, k, &mut p_reg, &mut s_reg);
            moments.sum_in_memory(&columns, paths, k, &mut p_mem, &mut s_mem);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&p_reg), bits(&p_mem), "{k} columns: products");
            assert_eq!(bits(&s_reg), bits(&s_mem), "{k} columns: sums");
        }
    }
}
