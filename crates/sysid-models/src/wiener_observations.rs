//! `I3` of the blind Wiener model on fixed trajectories, from sorted states.
//!
//! # Algorithm
//! `I3` depends on the trajectories only through the pairs `(z, y_i)` of every path and
//! step (`z` the first state), and each output's nonlinearity is piecewise linear in
//! `z` with the breakpoints as the only joints. Sorting the pairs by `z` once per
//! M-step and keeping the prefix sums of `y`, `y^2`, `w = y - z` and `w^2` turns the
//! residual sum of squares of either output into three range sums:
//!
//! ```text
//! saturation (b1 <= b2):  z < b1: (y - b1)^2,   b1 <= z <= b2: w^2,  z > b2: (y - b2)^2
//! dead zone  (b3 <= b4):  z < b3: (w + b3)^2,   b3 <= z <= b4: y^2,  z > b4: (w + b4)^2
//! ```
//!
//! with each square expanded (`sum (y - b)^2 = sum y^2 - 2 b sum y + n b^2`), and the
//! same sums give the gradient. The ranges are found by binary search with the
//! nonlinearities' own comparisons (`<` below, `<=` up to the upper breakpoint).
//!
//! **The exact maximiser.** For `lo <= hi` the sum separates: with `(v, c) = (y, w^2)`
//! (saturation) or `(-w, y^2)` (dead zone), `RSS(lo, hi) = lower(lo) + upper(hi)`,
//!
//! ```text
//! lower(b) = sum_{z < b} (b - v)^2 - C(z < b),   upper(b) = sum_{z > b} (b - v)^2 + C(z <= b)
//! ```
//!
//! (`C` the sum of `c`). Both are continuous and quadratic between consecutive sorted
//! `z`, so one scan over the segments (the segment's mean of `v`, clamped to it) finds
//! each side's global minimiser; where a side is flat (no state beyond the
//! breakpoint) the breakpoint is put at the data's edge. Then `r_i = RSS_i / n_i`.
//! When the two minimisers are not ordered the search gives up and BFGS runs.
//!
//! # Complexity
//! O(K T log(K T)) to prepare, O(log(K T)) per evaluation (against O(K T) for the
//! term-by-term sum), O(K T) for the exact maximiser. Expanding the squares loses about `log10(y^2 / r)` digits to
//! cancellation, ~3 at the study's `r = 0.01`: the value keeps ~13 significant digits.

use crate::wiener::Unpacked;
use sysid_em::gradient::ObservationSum;
use sysid_smc::{Series, Trajectories};

/// Prefix sums of `(y, y^2, w, w^2)` over pairs sorted by `z`, `w = y - z`.
struct SortedOutput {
    z: Vec<f64>,
    prefix: Vec<[f64; 4]>,
}

/// Which nonlinearity an output has, for the exact breakpoint search: the residual
/// below the lower breakpoint is `b - v` and the cost between the breakpoints is `c`,
/// with `(v, c) = (y, w^2)` for the saturation and `(-w, y^2)` for the dead zone.
#[derive(Clone, Copy)]
enum Kind {
    Saturation,
    DeadZone,
}

/// Sums over `[from, to)` of the sorted pairs.
struct RangeSums {
    count: f64,
    y: f64,
    yy: f64,
    w: f64,
    ww: f64,
}

impl SortedOutput {
    /// The pairs `(z, y)` whose `y` is not missing.
    fn new(mut pairs: Vec<(f64, f64)>) -> Self {
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut prefix = Vec::with_capacity(pairs.len() + 1);
        let mut running = [0.0; 4];
        prefix.push(running);
        for &(z, y) in &pairs {
            let w = y - z;
            running[0] += y;
            running[1] += y * y;
            running[2] += w;
            running[3] += w * w;
            prefix.push(running);
        }
        SortedOutput {
            z: pairs.into_iter().map(|(z, _)| z).collect(),
            prefix,
        }
    }

    fn len(&self) -> usize {
        self.z.len()
    }

    /// The three ranges `z < lo`, `lo <= z <= hi`, `z > hi`.
    fn split(&self, lo: f64, hi: f64) -> [RangeSums; 3] {
        let below = self.z.partition_point(|&z| z < lo);
        let up_to = below + self.z[below..].partition_point(|&z| z <= hi);
        [
            self.sums(0, below),
            self.sums(below, up_to),
            self.sums(up_to, self.len()),
        ]
    }

    /// The sums of `v` and `v^2` over `[from, to)`, and `c` over `[0, upto)`, for
    /// the output's `(v, c)` choice.
    fn v_sums(&self, from: usize, to: usize, kind: Kind) -> (f64, f64) {
        let r = self.sums(from, to);
        match kind {
            Kind::Saturation => (r.y, r.yy),
            Kind::DeadZone => (-r.w, r.ww),
        }
    }

    fn c_prefix(&self, upto: usize, kind: Kind) -> f64 {
        let r = self.sums(0, upto);
        match kind {
            Kind::Saturation => r.ww,
            Kind::DeadZone => r.yy,
        }
    }

    /// The minimiser and minimum of `lower(b) = sum_{z < b} (b - v)^2 - C(z < b)`.
    fn best_lower(&self, kind: Kind) -> (f64, f64) {
        let n = self.len();
        // no point below: lower = 0 for every b <= z_0; take the data's edge
        let mut best = (self.z[0], 0.0);
        for j in 1..=n {
            let (sv, svv) = self.v_sums(0, j, kind);
            let hi = if j < n { self.z[j] } else { f64::INFINITY };
            let b = (sv / j as f64).clamp(self.z[j - 1], hi);
            let value = svv - 2.0 * b * sv + j as f64 * b * b - self.c_prefix(j, kind);
            if value < best.1 {
                best = (b, value);
            }
        }
        best
    }

    /// The minimiser and minimum of `upper(b) = sum_{z > b} (b - v)^2 + C(z <= b)`.
    fn best_upper(&self, kind: Kind) -> (f64, f64) {
        let n = self.len();
        // no point above: upper = C(all) for every b >= z_{n-1}; take the data's edge
        let mut best = (self.z[n - 1], self.c_prefix(n, kind));
        for j in (0..n).rev() {
            let (sv, svv) = self.v_sums(j, n, kind);
            let above = (n - j) as f64;
            let lo = if j > 0 {
                self.z[j - 1]
            } else {
                f64::NEG_INFINITY
            };
            let b = (sv / above).clamp(lo, self.z[j]);
            let value = svv - 2.0 * b * sv + above * b * b + self.c_prefix(j, kind);
            if value < best.1 {
                best = (b, value);
            }
        }
        best
    }

    /// The breakpoints `(lo, hi)` minimising the residual sum of squares, and that
    /// sum; `None` when the two sides' minimisers are not ordered (then the sum is not
    /// separable) or the output has no data.
    fn best_breakpoints(&self, kind: Kind) -> Option<(f64, f64, f64)> {
        if self.len() == 0 {
            return None;
        }
        let (lo, lower) = self.best_lower(kind);
        let (hi, upper) = self.best_upper(kind);
        (lo < hi).then_some((lo, hi, lower + upper))
    }

    fn sums(&self, from: usize, to: usize) -> RangeSums {
        let (a, b) = (self.prefix[from], self.prefix[to]);
        RangeSums {
            count: (to - from) as f64,
            y: b[0] - a[0],
            yy: b[1] - a[1],
            w: b[2] - a[2],
            ww: b[3] - a[3],
        }
    }
}

/// `I3` of [`crate::WienerModel`] on fixed trajectories, prepared by sorting.
pub(crate) struct SortedObservations {
    outputs: [SortedOutput; 2],
    paths: f64,
}

impl SortedObservations {
    pub fn new(paths: &Trajectories, data: &Series) -> Self {
        let outputs = [0, 1].map(|i| {
            let mut pairs = Vec::with_capacity(paths.paths() * paths.steps());
            for t in 0..paths.steps() {
                let y = data.output(t)[i];
                if !y.is_nan() {
                    pairs.extend(paths.states(t).chunks_exact(2).map(|x| (x[0], y)));
                }
            }
            SortedOutput::new(pairs)
        });
        SortedObservations {
            outputs,
            paths: paths.paths() as f64,
        }
    }
}

impl ObservationSum for SortedObservations {
    fn value_and_gradient(&self, theta: &[f64], grad: &mut [f64]) -> f64 {
        let p = Unpacked::new(theta);
        let b = p.beta;
        let k = self.paths;
        // saturation: below and above, y - h = y - b
        let [below, middle, above] = self.outputs[0].split(b[0], b[1]);
        let e_below = below.y - below.count * b[0];
        let e_above = above.y - above.count * b[1];
        let rss_sat =
            below.yy - 2.0 * b[0] * below.y + below.count * b[0] * b[0] + middle.ww + above.yy
                - 2.0 * b[1] * above.y
                + above.count * b[1] * b[1];
        // dead zone: below and above, y - h = w + b
        let [below, middle, above] = self.outputs[1].split(b[2], b[3]);
        let e_below_dz = below.w + below.count * b[2];
        let e_above_dz = above.w + above.count * b[3];
        let rss_dead = below.ww
            + 2.0 * b[2] * below.w
            + below.count * b[2] * b[2]
            + middle.yy
            + above.ww
            + 2.0 * b[3] * above.w
            + above.count * b[3] * b[3];
        let n = [self.outputs[0].len() as f64, self.outputs[1].len() as f64];
        let rss = [rss_sat, rss_dead];
        grad[7] += (e_below + e_above) * p.inv_r[0] / k;
        grad[8] += e_above * p.inv_r[0] * p.gap_sat / k;
        grad[9] -= (e_below_dz + e_above_dz) * p.inv_r[1] / k;
        grad[10] -= e_above_dz * p.inv_r[1] * p.gap_dead / k;
        let mut value = 0.0;
        for i in 0..2 {
            grad[11 + i] += (-0.5 * n[i] + 0.5 * rss[i] * p.inv_r[i]) / k;
            value += n[i] * p.observation_norm[i] - 0.5 * rss[i] * p.inv_r[i];
        }
        value / k
    }

    /// The breakpoints by an exact search, then `r_i = RSS_i / n_i`.
    fn maximise(&self, theta: &mut [f64]) -> bool {
        let sat = self.outputs[0].best_breakpoints(Kind::Saturation);
        let dead = self.outputs[1].best_breakpoints(Kind::DeadZone);
        let (Some((b1, b2, rss1)), Some((b3, b4, rss2))) = (sat, dead) else {
            return false;
        };
        let r1 = rss1 / self.outputs[0].len() as f64;
        let r2 = rss2 / self.outputs[1].len() as f64;
        let entries = [b1, (b2 - b1).ln(), b3, (b4 - b3).ln(), r1.ln(), r2.ln()];
        if entries.iter().any(|v| !v.is_finite()) {
            return false;
        }
        theta[7..13].copy_from_slice(&entries);
        true
    }
}
